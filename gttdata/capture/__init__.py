"""Simulating an unsynchronized capture: timing, views, 2-D noise, missing observations, samples."""
