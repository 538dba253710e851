"""Tests of cosim.core."""
