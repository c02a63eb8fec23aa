"""The udev rules files shipped with spotlab (package data, no code).

This folder is mapped to the package ``spotlab.udev`` so that the rules travel
inside the wheel; ``spotlab.console.udev`` reads them with importlib.resources.
"""
