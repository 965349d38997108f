"""An example lfbench plugin: the tiny CNN ``tinycnn`` (lfbench_tiny.plugin)."""
