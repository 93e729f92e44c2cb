"""The axis driver: decision core, board session, lifecycle node and lifecycle tool."""
