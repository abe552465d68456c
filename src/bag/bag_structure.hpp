// The structure of a ROS1 bag (format 2.0), checked before librosbag reads it. librosbag trusts the offsets
// and lengths of the bag's index: an index entry that points outside its chunk, or a record length beyond the
// file, makes it read outside its buffers (a crash, not an exception). check_bag_structure walks the records
// librosbag will read - the bag header, the connection and chunk-info records at the index position, each
// chunk's header and the index-data records after it, and for every index entry the records it points to
// inside its chunk (decompressed for bz2 and lz4 chunks) - and checks every offset and length against the
// file or the chunk first.
#pragma once

#include <string>

namespace loopgate::bag {

// Throws BagError(file, what is wrong and at which byte offset) when the bag cannot be read safely.
void check_bag_structure(const std::string& file);

}  // namespace loopgate::bag
