"""Effects: what the returns become (drop, noise, intensity, materials, beam divergence, weather)."""
