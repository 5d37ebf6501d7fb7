"""Shipped attitude laws, installed as ``stationbed.controllers`` (DESIGN §7).

Each law is registered by name as an entry point of the group ``stationbed.controllers`` in
pyproject.toml; a package of your own can register its laws the same way, or a scene can name a
class directly as ``name = "your_module:YourClass"``. Write your own: subclass
:class:`stationbed.Controller` (see ``example_hold.py``).
"""
