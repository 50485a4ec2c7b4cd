"""Parameter identification by weighted least squares (eq. 5), simulation, calibrated URDF export."""
