"""Tests of cosim.campaign."""
