"""Small shared helpers: user-facing errors (errors), atomic writes (atomic), TOML reading and writing (tomlfile),
config sections declared once (options), what the machine can run and where tensors live (hardware)."""
