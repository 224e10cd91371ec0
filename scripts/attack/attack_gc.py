def packets(*a): pass
def order(*a): pass
def flood(*a): pass
def broadcast(*a): pass
