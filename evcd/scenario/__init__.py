"""Scenario building: road networks, charging stations and daily demand (no libsumo here)."""
