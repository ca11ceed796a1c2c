"""hexapod/backends package."""
