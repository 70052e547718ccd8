"""The sensor model: where the rays come from (presets in sensors.yaml, ray patterns, mirrors, platforms)."""
