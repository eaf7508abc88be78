"""Rigid registration of 2D images and 3D volumes (thesis ch. 2) by entropic measures of the joint histogram, with its
inputs, self-check, evaluation, synthetic misalignments, landscapes, reports and a SimpleITK reference. See
``docs/registration.md`` for the conventions and the measured accuracy and speed."""
