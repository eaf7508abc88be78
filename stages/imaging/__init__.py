"""Image files (2D images, 3D volumes, DICOM series): formats, header checks, reading with ITK's geometry;
used by the registration, kept apart from it as a generic reader of medical images."""
