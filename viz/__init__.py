"""Seeing what the swarm did: a drawing library (matplotlib, no Zenoh, no process).

Modules: ``geometry`` (positions of vertices and edges from Truth + Complex), ``coverage``
(pluggable coverage measure), ``figures`` (pure drawing), ``synth`` (a scripted stand-in
run for tests/demos), ``static`` (the live view's page). The commands that use it live in
swarmcover/ (``plot``, ``view``): swarmcover imports viz, never the other way round.
"""
