"""The safety supervisor: rules, core and node."""
