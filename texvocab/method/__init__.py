"""TexVocab itself: texture maps, vocabulary, encoder, pose feature, avatar field."""
