"""Nordic FCR prequalification: evaluate every TSO test file of an application (TR v1.1 Table 2).

The evaluation modules are pure (TsoLog and arrays in, frozen dataclasses out); result types in
:mod:`fcrlive.prequal.model`. See docs/prequal.md.
"""
