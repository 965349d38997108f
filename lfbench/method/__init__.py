"""The methods API: what a method is (:class:`Method`, :class:`Prediction`), the registry that names,
documents and creates them (``@register_method``, ``create``, spec strings), trainable networks
(:class:`Trainable`, ``@register_trainable``: what ``lfbench train``, ``ablate`` and ``bench`` use, and
what the generic :class:`NetworkMethod` runs as ``NAME:weights=PATH``), parameters declared with
``typing.Annotated`` (:class:`Range` bounds them) and the one checkpoint reader."""

from lfbench.method.base import Method, Prediction
from lfbench.method.network_method import NetworkMethod
from lfbench.method.params import Param, Range
from lfbench.method.registry import create, create_from_spec, list_methods, register_method
from lfbench.method.trainable import Trainable, get_trainable, register_trainable

__all__ = ["Method", "Prediction", "NetworkMethod", "Param", "Range", "create", "create_from_spec", "list_methods",
           "register_method", "Trainable", "get_trainable", "register_trainable"]
