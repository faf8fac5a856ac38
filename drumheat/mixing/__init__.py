"""drumheat.mixing"""
