"""Hardware bridge: live robots mixed into the simulated swarm through motion capture.

Pure cores: :mod:`hwbridge.frames` (mocap <-> world), :mod:`hwbridge.twin` (twin P-sync),
:mod:`hwbridge.safety` (clamp, deadman, geofence), :mod:`hwbridge.ros2` (CDR, ROS 2 keys),
:mod:`hwbridge.metrics`. Edges: :mod:`hwbridge.mocap` (sources), :mod:`hwbridge.output`,
:mod:`hwbridge.node` (``swarmcover hwbridge``), :mod:`hwbridge.fake_robot`
(``swarmcover fake-robot``). Configuration: :mod:`hwbridge.config`.
"""
