"""Co-simulation of plant FMUs with controllers: master, scenarios, results and the CLI."""

__version__ = "0.1.0"
