def future_items(*a): pass
def mixed_team(*a): pass
