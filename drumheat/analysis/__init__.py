"""drumheat.analysis"""
