"""The sensor boards: NMEA, MAX6675, VEML7700, switch debouncing, and their nodes."""
