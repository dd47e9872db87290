// A source of the consumer's own library (tests/package/consumer/CMakeLists.txt).
int consumer_part() { return 1; }
