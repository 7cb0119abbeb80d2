"""bearnav: certified bearing-only navigation controllers from a 2-D map."""

__version__ = "0.1.0"
