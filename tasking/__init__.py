"""tasking"""
