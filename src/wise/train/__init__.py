"""Training of the parameter prediction networks: data sets made on the fly and losses."""
