"""Sweeps, metrics, maximum-range estimation, reports and the command line."""
