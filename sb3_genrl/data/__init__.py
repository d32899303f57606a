"""sb3_genrl.data"""
