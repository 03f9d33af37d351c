"""Tests of evcd.sim: the SUMO driver and the charging FIFO."""
