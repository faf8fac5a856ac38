"""drumheat.experiments"""
