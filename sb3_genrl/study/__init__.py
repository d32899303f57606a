"""sb3_genrl.study"""
