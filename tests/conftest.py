"""Pytest configuration: fixture modules shared by every test package."""

pytest_plugins = ["tests.fixtures.scenes", "tests.fixtures.mocap"]
