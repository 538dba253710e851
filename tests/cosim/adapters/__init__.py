"""Tests, mirroring the packages (docs: guide/regression.md)."""
