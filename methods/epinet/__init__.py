"""EPINET (Shin et al., CVPR 2018): the authors' multi-stream network (network.py), the trainable network
``epinet`` (trainable.py; its method is lfbench's generic network method, ``epinet:weights=PATH``) and the
import of the authors' Keras checkpoints (keras_import.py, through ``lfbench convert-keras``). Light at
import: torch comes with network.py."""
