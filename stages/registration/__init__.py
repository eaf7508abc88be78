"""Rigid 2D image registration (thesis ch. 2): image io, rigid transforms in ITK's convention,
interpolation, joint histograms, entropic divergences (Jensen-Tsallis, Jensen-Renyi, MI,
Tsallis MI), SPSA and Powell optimisers, coarse-to-fine registration, evaluation against a
known transform, synthetic misalignments, objective landscapes and a SimpleITK reference.

See ``docs/registration.md`` for the conventions and the measured accuracy and speed.
"""
