"""Training any registered trainable network (lfbench.method.trainable; SubFocal by default): TOML
configs, the authors' patch sampling and augmentation, the two-stage loop with atomic checkpoints and
resume, and distributed data-parallel training.

Modules: config (TrainConfig from TOML: every option declared once), reference (docs/training-config.md from
those declarations), data (scenes in memory, patch sampling), augment (gamma, flip, rotation, noise with the
angular axes), distributed (torch.distributed setup), checkpoint (atomic save / weights-only load), validate
(BadPix / MSE on chosen scenes), losses, curves (the run's loggers), loop (``train``: setup, resume, build,
fit, export).
"""
