"""drumheat.motion"""
