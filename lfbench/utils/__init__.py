"""Small shared helpers: user-facing errors (errors), atomic writes (atomic), TOML reading (tomlfile), what the
machine can run and where tensors live (hardware)."""
