"""drumheat.results"""
