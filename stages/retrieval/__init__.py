"""Shape retrieval: PSB retrieval metrics (:mod:`.metrics`) and baseline descriptors (:mod:`.baselines`: D2, spherical harmonics, ShapeDNA)."""
