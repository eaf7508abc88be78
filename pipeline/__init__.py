"""topomatch engine: configs, stage registry, runner, cache, executors, reports and CLI."""


