"""The coordinator's angle helpers are the ground floor's (``ground.angles``): one wrap."""
from ground.angles import angle_between, circular_mean, side, side_array, wrap, wrap_array

__all__ = ["wrap", "wrap_array", "angle_between", "circular_mean", "side", "side_array"]
