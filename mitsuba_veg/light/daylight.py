def daylight(*a, **k):  # placeholder, replaced by the daylight model
    raise NotImplementedError
