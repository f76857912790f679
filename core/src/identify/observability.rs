//! (placeholder: identifiability and uncertainty, being written)
