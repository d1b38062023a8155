"""Test kits that ship with the package, for the project's tests and benchmarks and for users testing their own
plug-ins: ``synthetic`` (analytic scenes with exact ray casts, camera images encoded as the renderer would) and
``fakes`` (tiny deterministic stand-in ring members with fault injection, for runtime tests). Importing the
package imports nothing else.
"""
