"""shields package."""
