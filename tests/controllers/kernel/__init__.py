"""Tests of controllers.kernel."""
