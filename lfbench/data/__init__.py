"""Data: light-field scenes in the HCI layout (scene), PFM maps (pfm), camera parameters (params),
benchmark submissions and their validation (submission, submission_check), the synthetic generator
(synth) and sub-pixel view shifting (shift)."""
