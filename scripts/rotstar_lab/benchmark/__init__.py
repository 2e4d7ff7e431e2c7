"""Measurements behind `make bench` (scripts/bench.py)"""
