"""OpenCL C sources of rsocl (package data; read with importlib.resources)."""
