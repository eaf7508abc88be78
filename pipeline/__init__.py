"""topomatch engine: configs, stage registry, runner, cache, executors, reports and CLI."""

__version__ = "0.1.0"
