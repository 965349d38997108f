"""DistgDisp (Wang et al., TPAMI 2022): the authors' network (network.py), their computation as a
straightforward reference (reference.py), the trainable network ``distgdisp`` (trainable.py) and the
loading of their released ``.pth.tar`` checkpoints. Light at import: torch comes with network.py."""
