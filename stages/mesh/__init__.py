"""Mesh stages: io, clean/validate, decimate, noise, transform, measures."""
