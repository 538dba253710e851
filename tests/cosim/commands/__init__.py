"""Tests of cosim.commands."""
