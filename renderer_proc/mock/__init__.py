"""The mock backend: the same buffers as the GL one from the exact ray cast, no OpenGL."""
