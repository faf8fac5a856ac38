"""drumheat.thermal"""
