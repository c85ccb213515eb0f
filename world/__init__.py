"""The world simulator: maps, pymunk physics, emulated bearing cameras and touch, clock.

Pure parts (no Zenoh, importable by any component):
  * :mod:`world.config`      -- run-config TOML/ROS-YAML loading into frozen dataclasses;
  * :mod:`world.maps`        -- WorldMap (polygons, wall segments, free space), ROS loader;
  * :mod:`world.sensing`     -- vectorised camera (bearings, occlusion) and touch sensors;
  * :mod:`world.physics`     -- pymunk space wrapper (spawn, commands, step);
  * :mod:`world.groundtruth` -- coverage fraction and ideal triangular-lattice counts;
  * :mod:`world.clock`       -- lockstep and real-time pacing logic.
The process is :mod:`world.node` (``swarmcover world CONFIG``).
"""
