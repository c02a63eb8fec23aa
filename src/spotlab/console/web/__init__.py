"""The web console of ``spotlab console``."""
