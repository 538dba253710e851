"""Tests of controllers.certification."""
