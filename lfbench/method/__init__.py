"""The methods API: what a method is (:class:`Method`, :class:`Prediction`) and the registry that
names, documents and creates them (``@register_method``, ``create``, spec strings)."""

from lfbench.method.base import Method, Prediction
from lfbench.method.registry import create, create_from_spec, list_methods, method_info, register_method

__all__ = ["Method", "Prediction", "create", "create_from_spec", "list_methods", "method_info", "register_method"]
