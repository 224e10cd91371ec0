def lines(*a): pass
def long_lines(*a): pass
def half_lines(*a): pass
def connections(*a): pass
def no_reader(*a): pass
def config_files(*a): pass
