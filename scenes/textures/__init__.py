"""The built-in scenes' textures (package data; generate.py makes them)."""
