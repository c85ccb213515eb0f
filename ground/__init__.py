"""The ground floor: what every room of the house needs, written once.

``ground.angles`` (wrap, circular mean, sides); ``ground.geometry`` (closed rings to wall
segments); ``ground.toml`` (the TOML writer). Pure functions, no I/O, numpy only where
an array is asked for: light enough for every process, an agent included.
"""
