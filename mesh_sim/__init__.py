"""mesh_sim"""
