"""``planesweep``: lfbench's training-free disparity estimator. The registered method (method.py, light
at import) and its torch estimator (estimator.py: the pipeline, step by step)."""
