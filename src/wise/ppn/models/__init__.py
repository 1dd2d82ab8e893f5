"""The built-in global parameter prediction models, one safetensors file per effect."""
