"""Battery physics: cell models, thermal models (thermal.py) and their verification."""
