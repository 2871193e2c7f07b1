"""Desktop viewer for texvocab avatars (moderngl + imgui-bundle)."""
