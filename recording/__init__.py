"""Recordings of a swarm's key space: MCAP files that Foxglove, Lichtblick and the ``mcap``
tools open, and their replay onto a live bus.

* :mod:`recording.record`: the recorder (``swarmcover record``), one JSON channel per Zenoh
  key with its schema from bus/messages.py, liveliness tokens, world/info once, and the
  Foxglove scene;
* :mod:`recording.replay`: reading a recording back (``read_messages``) and republishing it
  with its original timing (``swarmcover replay``);
* :mod:`recording.scene`: the ``foxglove.SceneUpdate`` of one moment of a run (walls,
  sources, robots, Rips edges, frontier and obstacle edges), for recordings and the live
  Foxglove/Lichtblick view.

A floor of its own (tests/test_layers.py): it imports the bus, the ground floor and the
drawing library (viz), never the commands (swarmcover) or the simulator, agents and
coordinator.
"""
