"""anisognn: graph network surrogate (not built yet, see issue 3)."""
