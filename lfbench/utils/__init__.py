"""Small shared helpers: user-facing errors (errors), atomic writes (atomic), TOML reading (tomlfile)."""
