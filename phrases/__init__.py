"""What Kaspar says: one TOML file per language, shipped as package data."""
