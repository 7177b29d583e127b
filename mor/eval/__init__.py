"""The evaluation layer: the protocol (methods, episode seeds, per-episode records, statistics) and the results
card. Above ``mor.policy``; nothing below imports it."""
