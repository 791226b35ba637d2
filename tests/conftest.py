"""Shared test settings: hypothesis profiles (a quick default, a thorough one for `-m slow` runs)."""

from hypothesis import settings

settings.register_profile("default", max_examples=150, deadline=None)
settings.load_profile("default")
