"""One thin module per DVC stage: read parameters and inputs, call ``mor``, write outputs. No logic here."""
