def sun_position(*a, **k):  # placeholder, replaced by the SPA implementation
    raise NotImplementedError


def sun_direction(*a, **k):
    raise NotImplementedError
