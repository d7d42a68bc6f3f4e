"""The object twin: the mounted object's pose offset and reflectance from its frames (issue 14)."""
