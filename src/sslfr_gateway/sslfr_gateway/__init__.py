"""The plant gateway: SunSpec over Modbus TCP (models 1, 601, 302) and Foxglove live."""
