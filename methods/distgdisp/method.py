"""Registers the trainable network ``distgdisp`` (its method is lfbench's generic network method:
``distgdisp:weights=FILE``, an lfbench weights file or the authors' released ``.pth.tar``)."""

from lfbench_methods.distgdisp.trainable import DistgDispTrainable  # noqa: F401 (registers it)
