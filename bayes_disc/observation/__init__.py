"""Observations: marker data files, simulation cases, synthetic flights, configuration reading."""
from .config_io import ConfigError
from .markers import (FlightObservation, MarkerFileError, MarkerTable, flights_from_table, load_flights,
                      read_marker_csv, table_from_flights, write_marker_csv)

__all__ = ["ConfigError", "FlightObservation", "MarkerFileError", "MarkerTable", "flights_from_table",
           "load_flights", "read_marker_csv", "table_from_flights", "write_marker_csv"]
