"""A local web editor for parameters and parameter masks (``wise edit``).

:mod:`wise.editor.brush` paints strokes on masks, :mod:`wise.editor.session` holds one
browser session's image, effect, masks and history, :mod:`wise.editor.app` serves the page
and its API, :mod:`wise.editor.server` starts it.
"""
