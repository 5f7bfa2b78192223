"""The built-in scenes' meshes (package data; generate.py makes them)."""
