// MCAP reader (https://mcap.dev/spec, major version 0): the container ROS 2 records to by default.
// A streamed reader of the data section: Header, Schema, Channel, Message, Attachment, Metadata
// and Data End records in file order, Chunks expanded (compression "", "lz4" frames, "zstd"),
// Message Index records skipped; the summary section (indexes and statistics for random access)
// is not read. Every checksum the file provides is checked (the data section's, each chunk's
// uncompressed records, each attachment's). Unknown and private opcodes are skipped, fields added
// at the end of known records are ignored (both as the specification asks). Every length and count
// is checked against the bytes that remain before anything is allocated from it; a malformed
// file gives one ts::Error naming the file and the record ("record 7 (Chunk) at byte 1043:
// compression").
//
// Checked against the MCAP specification's 416 conformance files (tests/io/mcap_conformance, rebuilt
// byte for byte by scripts/mcap_conformance.py): every file's data-section records equal the
// expected ones.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <span>
#include <string>
#include <vector>

namespace ts::io {

struct McapHeader {
  std::string profile;   ///< "ros2" for rosbag2 recordings
  std::string library;
};

struct McapSchema {
  std::uint16_t id = 0;
  std::string name;       ///< e.g. "geometry_msgs/msg/PoseStamped"
  std::string encoding;   ///< e.g. "ros2msg"
  std::vector<std::uint8_t> data;
};

struct McapChannel {
  std::uint16_t id = 0;
  std::uint16_t schema_id = 0;        ///< 0: no schema
  std::string topic;
  std::string message_encoding;       ///< e.g. "cdr"
  std::map<std::string, std::string> metadata;
};

struct McapMessage {
  std::uint16_t channel_id = 0;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0;         ///< ns
  std::uint64_t publish_time = 0;     ///< ns
  std::span<const std::uint8_t> data; ///< valid during the callback only
};

struct McapAttachment {
  std::uint64_t log_time = 0, create_time = 0;
  std::string name, media_type;
  std::span<const std::uint8_t> data; ///< valid during the callback only
};

struct McapMetadata {
  std::string name;
  std::map<std::string, std::string> metadata;
};

/// What the reader hands over, in file order (any may be empty).
struct McapHandlers {
  std::function<void(const McapHeader&)> header = {};
  std::function<void(const McapSchema&)> schema = {};
  std::function<void(const McapChannel&)> channel = {};
  std::function<void(const McapMessage&)> message = {};
  std::function<void(const McapAttachment&)> attachment = {};
  std::function<void(const McapMetadata&)> metadata = {};
};

struct McapReadSummary {
  std::uint64_t records = 0;          ///< data-section records read (chunk contents counted)
  std::uint64_t chunks = 0;
  std::uint64_t messages = 0;
  std::uint32_t data_section_crc = 0; ///< as stored in Data End (0: none given)
  bool data_end = false;              ///< the file has a Data End record (and was checked)
};

/// Stream the data section of an MCAP file through `handlers`. Throws ts::Error naming the file
/// and the record for a missing file, bad magic, a truncated or malformed record, an unknown
/// chunk compression, or a checksum that does not match. A schema or channel id referenced
/// before it was defined is an error naming the message.
McapReadSummary read_mcap(const std::filesystem::path& path, const McapHandlers& handlers);

/// One message to write (write_mcap): its channel, times and CDR (or other) bytes.
struct McapOutMessage {
  std::uint16_t channel_id = 0;
  std::uint32_t sequence = 0;
  std::uint64_t log_time = 0, publish_time = 0;
  std::vector<std::uint8_t> data;
};

/// Write a small MCAP file (tests and tools that make recordings): the header, the schemas and
/// channels, then the messages unchunked, the Data End record with the data section's CRC32 and
/// an empty summary. Throws ts::Error naming the file when it cannot be written.
void write_mcap(const std::filesystem::path& path, const McapHeader& header, const std::vector<McapSchema>& schemas,
                const std::vector<McapChannel>& channels, const std::vector<McapOutMessage>& messages);

/// The compressions the reader inflates: "", "lz4", "zstd".
const std::vector<std::string>& mcap_compressions();

}  // namespace ts::io
