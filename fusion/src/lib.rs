//! fusion: geometry, pose and ball EKFs, local and global world models.
//! (Being built: see issue "World models".)
