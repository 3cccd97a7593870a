"""mesh_sim/bench"""
