"""The science of topomatch, one concept per module, grouped by domain."""
