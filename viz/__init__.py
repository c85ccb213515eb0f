"""Seeing what the swarm did: figures (matplotlib, no Zenoh), plots of a run, live view.

Modules: ``geometry`` (positions of vertices and edges from Truth + Complex), ``coverage``
(pluggable coverage measure), ``figures`` (pure drawing), ``plot`` (``swarmcover plot``),
``view`` (``swarmcover view``, browser), ``synth`` (a scripted stand-in run for tests/demos).
"""
