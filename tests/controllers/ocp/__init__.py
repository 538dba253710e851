"""Tests of controllers.ocp."""
