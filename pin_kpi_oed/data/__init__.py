"""File formats and containers: measurement sets (CSV), importers, atomic writes."""
