"""YAML in: the scenario loader with file:line:col marks, the JSON Schema and the typed records (``config``)."""
