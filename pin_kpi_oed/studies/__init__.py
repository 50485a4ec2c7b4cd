"""The paper's studies (KUKA cells, 90 notional arms) and Monte-Carlo / real-data validation."""
