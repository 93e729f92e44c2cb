"""The recorded day of the SSLFR tracker: the bag library (bag/), the recorder node and
the commands that record, inspect, replay, compare (what-if) and report a day."""
