"""lfbench's built-in methods (installed as the package ``lfbench_methods``).

Each module registers its methods with ``@register_method`` and is listed in the
``lfbench.methods`` entry-point group of pyproject.toml, the same way a third-party plugin is.
"""
