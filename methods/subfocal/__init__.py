"""SubFocal (Chao et al., TCI 2023) and its baseline LFattNet: network (network.py), Keras checkpoint
import, whole-image and exactly tiled inference, the trainable networks and the registered methods
``subfocal`` / ``lfattnet``. Light at import: torch comes with network.py."""
