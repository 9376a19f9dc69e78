"""Importers: real floor plans (ROS occupancy grids, GeoJSON) into Bearings map files."""
