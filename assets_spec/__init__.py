"""What external files must contain: JSON specs read by texvocab.io.spec, READMEs for people.
Installed as the package ``texvocab.assets_spec`` (see pyproject.toml)."""
