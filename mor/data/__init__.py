"""The data pipeline: episode MCAP records, collection, manifest and splits, LeRobot datasets, validation, cards."""
