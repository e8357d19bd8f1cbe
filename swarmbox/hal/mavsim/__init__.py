"""mavsim"""
