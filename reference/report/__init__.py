"""The accuracy report: the whole job and its HTML, Markdown and JSON pages (build), and
the pages' image viewer (viewer)."""
