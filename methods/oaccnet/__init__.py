"""OACC-Net (Wang et al., CVPR 2022): the network (network.py: the authors' layers and key names, the
occlusion-aware cost constructor without unfolding, two-pass inference) and the trainable network
``oaccnet`` (trainable.py; also loads the authors' released ``.pth.tar``). Light at import."""
