"""SubFocal (Chao et al., TCI 2023) and its baseline LFattNet: network, Keras checkpoint import,
whole-image and exactly tiled inference, and the registered methods ``subfocal`` / ``lfattnet``."""

from lfbench_methods.subfocal.network import SubFocalNet, count_trainable

__all__ = ["SubFocalNet", "count_trainable"]
