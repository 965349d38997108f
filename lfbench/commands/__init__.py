"""Subcommands of the ``lfbench`` CLI, one module each."""
