"""Tests, mirroring the packages (see the README and docs: "Regression tests")."""
