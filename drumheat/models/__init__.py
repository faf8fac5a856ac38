"""drumheat.models"""
