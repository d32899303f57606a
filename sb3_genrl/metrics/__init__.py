"""sb3_genrl.metrics"""
