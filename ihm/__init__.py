"""ihm package."""
