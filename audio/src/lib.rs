//! audio: the 72-tone acoustic messaging codec.
//! (Being built: see issue "Acoustic messaging".)
