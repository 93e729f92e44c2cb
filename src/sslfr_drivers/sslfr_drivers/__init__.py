"""SSLFR drivers: board protocol and links, axis/sensor driver nodes, safety supervisor, simulated boards."""
